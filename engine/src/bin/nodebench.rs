//! `nodebench`: the headless node-generation benchmark. Prints Markdown tables, optionally writes
//! JSON rows and a speed-against-error plot. See `--help`.

use anyhow::{Context, Result, bail};
use clap::Parser;
use engine::bounds::{self, BoundsCache};
use engine::measure::{self, ViewError};
use engine::mesh::{self, NodeMesh};
use engine::quadtree::{NodeKey, QuadTree};
use engine::select::{Camera, SelectParams, Selection, select};
use engine::tiles::{Tile, TileCache, TileKey};
use engine::tin;
use engine::world::World;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

const SECTIONS: [&str; 6] = [
    "tiles",
    "terrain",
    "selection",
    "error",
    "vegetation",
    "streaming",
];

/// Node-generation benchmark: speed of every CPU phase and speed against measured error.
///
/// Sections: `tiles` (16 m tile generation), `terrain` (node bounds, grid mesh, TIN mesh),
/// `selection` (per-frame quad-tree selection along a flight), `error` (triangles against
/// measured on-screen pixel error for tau in {0.5, 1, 2, 4, 8}, for the grid, the TIN and a
/// CDLOD-style distance selection tuned to the same measured error), `vegetation` (kept points per
/// second of the ranked Poisson tile against Bridson sampling from the `fast_poisson` crate,
/// vegetation phase time per node, instances and draw calls per frame on the flight),
/// `streaming` (real-time
/// flights at 50, 150 and 300 m/s through the streaming system: request-to-ready latency,
/// cancelled jobs, pop debt). Per-item times are on one
/// core (p50/p95/max); throughput is given for 1 and N worker threads.
#[derive(Parser)]
#[command(name = "nodebench", version, about, long_about)]
struct Cli {
    /// Map folder (the default map is generated there on first use if missing).
    #[arg(long, default_value = "maps/default")]
    map: PathBuf,
    /// Run only these sections (comma-separated): tiles, terrain, selection, error, vegetation,
    /// streaming.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// A few seconds in total: fewer items, cameras and thresholds (used by the test script).
    #[arg(long)]
    quick: bool,
    /// Write the rows as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the speed-against-error plot (PNG) here.
    #[arg(long, default_value = "target/nodebench/speed_vs_error.png")]
    plot: PathBuf,
    /// Worker threads for the throughput rows (default: all cores).
    #[arg(long)]
    workers: Option<usize>,
    /// Viewport height in pixels for selection and error (width is 16:9).
    #[arg(long, default_value_t = 720)]
    viewport_height: u32,
}

#[derive(serde::Serialize)]
struct Row {
    section: String,
    metric: String,
    value: f64,
    unit: String,
    params: String,
}

struct Report {
    rows: Vec<Row>,
}

impl Report {
    fn add(&mut self, section: &str, metric: &str, value: f64, unit: &str, params: &str) {
        self.rows.push(Row {
            section: section.into(),
            metric: metric.into(),
            value,
            unit: unit.into(),
            params: params.into(),
        });
    }

    /// p50 / p95 / max rows of a list of per-item durations (seconds).
    fn timings(&mut self, section: &str, what: &str, mut secs: Vec<f64>, params: &str) {
        secs.sort_by(f64::total_cmp);
        let q = |p: f64| secs[((secs.len() - 1) as f64 * p).round() as usize];
        if secs.is_empty() {
            return;
        }
        self.add(section, &format!("{what} p50"), q(0.5) * 1e6, "µs", params);
        self.add(section, &format!("{what} p95"), q(0.95) * 1e6, "µs", params);
        self.add(section, &format!("{what} max"), q(1.0) * 1e6, "µs", params);
    }

    fn print_markdown(&self) {
        println!("| section | metric | value | unit | params |\n|---|---|---:|---|---|");
        for r in &self.rows {
            let v = if r.value.abs() >= 100.0 || r.value == r.value.round() {
                format!("{:.0}", r.value)
            } else {
                format!("{:.3}", r.value)
            };
            println!(
                "| {} | {} | {} | {} | {} |",
                r.section, r.metric, v, r.unit, r.params
            );
        }
    }
}

fn bar(len: u64, msg: &str) -> ProgressBar {
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template("{msg:24} [{bar:30}] {pos}/{len} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    b.set_message(msg.to_string());
    b
}

/// Items per second with `workers` threads each doing `per_worker` calls of `f`.
fn throughput(workers: usize, per_worker: usize, f: &(dyn Fn(usize) + Sync)) -> f64 {
    let t0 = Instant::now();
    std::thread::scope(|s| {
        for w in 0..workers {
            s.spawn(move || {
                for i in 0..per_worker {
                    f(w * per_worker + i);
                }
            });
        }
    });
    (workers * per_worker) as f64 / t0.elapsed().as_secs_f64()
}

fn random_tile(world: &World, i: usize) -> TileKey {
    let s = world.size_m();
    let u = worldgen::noise::unit3(0xB1, i as i64, 0);
    let v = worldgen::noise::unit3(0xB1, i as i64, 1);
    TileKey {
        tx: (u * s[0] / 16.0) as i32,
        ty: (v * s[1] / 16.0) as i32,
    }
}

fn section_tiles(world: &World, r: &mut Report, quick: bool, workers: usize) {
    let n = if quick { 30 } else { 300 };
    let b = bar(n as u64, "tiles");
    let mut times = Vec::with_capacity(n);
    for i in 0..n {
        let t0 = Instant::now();
        std::hint::black_box(Tile::generate(world, random_tile(world, i)));
        times.push(t0.elapsed().as_secs_f64());
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!(
        "{n} tiles, {} samples each",
        engine::tiles::TILE_SAMPLES.pow(2)
    );
    r.timings("tiles", "16 m tile generation", times, &params);
    let per = if quick { 10 } else { 100 };
    for w in [1, workers] {
        let tps = throughput(w, per, &|i| {
            std::hint::black_box(Tile::generate(world, random_tile(world, 10_000 + i)));
        });
        r.add(
            "tiles",
            &format!("throughput, {w} worker(s)"),
            tps,
            "tiles/s",
            "",
        );
    }
}

/// Nodes a flight would draw at tau = 2 px (a realistic mix of levels).
fn flight_nodes(world: &World, tree: &QuadTree, cams: &[Camera], limit: usize) -> Vec<NodeKey> {
    let mut cache = BoundsCache::new();
    let mut keys: Vec<NodeKey> = Vec::new();
    for cam in cams {
        let s = select(
            world,
            tree,
            &mut cache,
            cam,
            SelectParams {
                tau_px: 2.0,
                max_level: tree.max_level,
                cull: true,
            },
        );
        keys.extend(s.nodes.iter().map(|n| n.key));
    }
    keys.sort();
    keys.dedup();
    // Spread the sample over the list, deterministically.
    let step = (keys.len() / limit.max(1)).max(1);
    keys.into_iter().step_by(step).take(limit).collect()
}

fn section_terrain(
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
    // Per node as in the engine (the parent's bounds are known when a node is measured).
    let (mut raised, mut ratio_sum) = (0usize, 0.0f64);
    for &k in &keys {
        let t0 = Instant::now();
        let own = bounds::measure(world, tree, k);
        t_bounds.push(t0.elapsed().as_secs_f64());
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
    r.timings("terrain", "node bounds (error + AABB)", t_bounds, &params);
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
    // Cold caches per node, except the ancestors' bounds (always known first in the engine).
    let mut ancestors = BoundsCache::new();
    for &k in &keys {
        if let Some(p) = k.parent() {
            ancestors.get(world, tree, p);
        }
    }
    for &k in &keys {
        ancestors.remove(k);
    }
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

fn section_vegetation(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
) {
    use engine::vegetation::{self as veg, Placer};
    let placer = Placer::new(world);
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
                    let rect = engine::world::Rect {
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
    // 2. The vegetation phase per node (placement, heights, exclusions, representation and
    // grouping), for the nodes a flight draws at tau 2.
    let keys = flight_nodes(
        world,
        tree,
        &cams[..cams.len().min(if quick { 2 } else { 16 })],
        if quick { 24 } else { 240 },
    );
    let b = bar(keys.len() as u64, "vegetation nodes");
    let mut times = Vec::new();
    let mut instances = 0usize;
    for &k in &keys {
        let t0 = Instant::now();
        let v = veg::node_vegetation(world, &placer, tree, k);
        times.push(t0.elapsed().as_secs_f64());
        instances += v.instances();
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!("{} nodes from the flight at tau 2", keys.len());
    r.timings("vegetation", "node vegetation phase", times, &params);
    r.add(
        "vegetation",
        "instances per node (mean)",
        instances as f64 / keys.len().max(1) as f64,
        "instances",
        &params,
    );
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
            SelectParams {
                tau_px: 2.0,
                max_level: tree.max_level,
                cull: true,
            },
        );
        let mut ancestors: Vec<NodeKey> = Vec::new();
        let (mut n_inst, mut n_draw) = (0usize, 0usize);
        let mut count = |v: &veg::NodeVegetation, only_kept: bool, by_rep: &mut [usize; 3]| {
            for g in &v.groups {
                if only_kept && g.replaced_on_split {
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
                .or_insert_with(|| veg::node_vegetation(world, &placer, tree, n.key));
            count(v, false, &mut by_rep);
            let mut k = n.key;
            while let Some(p) = k.parent() {
                ancestors.push(p);
                k = p;
            }
        }
        ancestors.sort();
        ancestors.dedup();
        for a in ancestors {
            let v = veg_cache
                .entry(a)
                .or_insert_with(|| veg::node_vegetation(world, &placer, tree, a));
            count(v, true, &mut by_rep);
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
        v.get(v.len() / 2).copied().unwrap_or(0.0)
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

    // 4. Splitting less behind dense vegetation, on the low half of the automatic flyover
    // (25 m above the valley floor): nodes and triangles with and without, at tau 2.
    let canopy = veg::Canopy::new(world, &placer);
    let vp = cams[0].viewport_px;
    let n_low: u32 = if quick { 4 } else { 48 };
    for walk in [false, true] {
        let low: Vec<Camera> = (0..n_low)
            .map(|i| {
                let mut c =
                    engine::app::auto_flyover(world, 0.5 * f64::from(i) / f64::from(n_low), vp);
                if walk {
                    // The same track at eye height, 1.8 m above the ground.
                    let p = c.position_m;
                    c.position_m.z = world.height_m(p.x, p.y) + 1.8;
                }
                c
            })
            .collect();
        let p = SelectParams {
            tau_px: 2.0,
            max_level: tree.max_level,
            cull: true,
        };
        let (mut plain_nodes, mut occl_nodes, mut hidden, mut t_plain, mut t_occl) =
            (0usize, 0usize, 0usize, 0.0f64, 0.0f64);
        let mut worst_visible_px = 0.0f64;
        for cam in &low {
            // Bounds first, so the timings compare the traversals only.
            let _ = select(world, tree, &mut cache, cam, p);
            let _ = engine::select::select_occluded(world, tree, &mut cache, cam, p, Some(&canopy));
            let t0 = Instant::now();
            let a = select(world, tree, &mut cache, cam, p);
            t_plain += t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            let b = engine::select::select_occluded(world, tree, &mut cache, cam, p, Some(&canopy));
            t_occl += t0.elapsed().as_secs_f64();
            plain_nodes += a.nodes.len();
            occl_nodes += b.nodes.len();
            for n in &b.nodes {
                if n.error_px > p.tau_px && n.key.level < tree.max_level {
                    hidden += 1;
                    let f = canopy.error_factor(
                        world,
                        cam.position_m,
                        tree.rect(n.key),
                        n.bounds.z_max_m,
                        n.dist_m,
                    );
                    worst_visible_px = worst_visible_px.max(n.error_px * f);
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
            "occlusion: largest visible error of those (px x visibility)",
            worst_visible_px,
            "px",
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

fn triangles(sel: &Selection) -> usize {
    // Grid nodes: 32 x 32 x 2 surface + 4 x 32 x 2 skirt triangles.
    sel.nodes.len() * (2048 + 256)
}

fn section_selection(world: &World, tree: &QuadTree, cams: &[Camera], r: &mut Report, quick: bool) {
    let mut cache = BoundsCache::new();
    let taus: &[f64] = if quick { &[2.0] } else { &[1.0, 2.0, 4.0] };
    for &tau in taus {
        let p = SelectParams {
            tau_px: tau,
            max_level: tree.max_level,
            cull: true,
        };
        let b = bar(cams.len() as u64, &format!("selection tau {tau}"));
        let t0 = Instant::now();
        let before = cache.computed;
        for cam in cams {
            select(world, tree, &mut cache, cam, p);
            b.inc(1);
        }
        b.finish_and_clear();
        let cold_s = t0.elapsed().as_secs_f64();
        let params = format!(
            "tau {tau} px, {} cameras, {}x{}",
            cams.len(),
            cams[0].viewport_px[0],
            cams[0].viewport_px[1]
        );
        r.add(
            "selection",
            "first pass incl. node bounds",
            cold_s * 1e3,
            "ms",
            &format!("{params}, {} bounds measured", cache.computed - before),
        );
        let mut times = Vec::new();
        let (mut nodes, mut tris, mut over) = (0usize, 0usize, 0u32);
        let reps = if quick { 3 } else { 10 };
        for _ in 0..reps {
            for cam in cams {
                let t = Instant::now();
                let s = select(world, tree, &mut cache, cam, p);
                times.push(t.elapsed().as_secs_f64());
                nodes += s.nodes.len();
                tris += triangles(&s);
                over += s.over_tau_at_finest;
            }
        }
        let frames = (reps * cams.len()) as f64;
        r.timings(
            "selection",
            "selection per frame (bounds cached)",
            times,
            &params,
        );
        r.add(
            "selection",
            "nodes per frame",
            nodes as f64 / frames,
            "nodes",
            &params,
        );
        r.add(
            "selection",
            "triangles per frame",
            tris as f64 / frames,
            "triangles",
            &params,
        );
        r.add(
            "selection",
            "finest nodes still over tau",
            f64::from(over) / frames,
            "nodes",
            &params,
        );
    }
}

/// Node meshes (grid and TIN) built once and reused across thresholds and bisection steps.
#[derive(Default)]
struct MeshCache {
    grid: std::collections::HashMap<NodeKey, NodeMesh>,
    tin: std::collections::HashMap<NodeKey, NodeMesh>,
}

impl MeshCache {
    fn grid(
        &mut self,
        world: &World,
        tree: &QuadTree,
        cache: &mut BoundsCache,
        tiles: &mut TileCache,
        key: NodeKey,
    ) -> &NodeMesh {
        self.grid
            .entry(key)
            .or_insert_with(|| mesh::build_with_tiles(world, tree, cache, tiles, key))
    }

    fn tin(
        &mut self,
        world: &World,
        tree: &QuadTree,
        cache: &mut BoundsCache,
        tiles: &mut TileCache,
        key: NodeKey,
        target: f64,
    ) -> &NodeMesh {
        if !self.tin.contains_key(&key) {
            let g = self.grid(world, tree, cache, tiles, key);
            let t = tin::build(g, target * g.bounds.error_m).0;
            self.tin.insert(key, t);
        }
        &self.tin[&key]
    }
}

/// Builds meshes for a selection (optionally as TINs) and measures the view's pixel error.
fn measure_view(
    world: &World,
    tree: &QuadTree,
    ctx: &mut (BoundsCache, TileCache, MeshCache),
    cam: &Camera,
    sel: &Selection,
    per_side: u32,
    tin_target: Option<f64>,
) -> (usize, ViewError) {
    let (cache, tiles, meshes_cache) = ctx;
    let mut meshes = Vec::with_capacity(sel.nodes.len());
    let mut tris = 0;
    for s in &sel.nodes {
        let m = match tin_target {
            Some(f) => meshes_cache
                .tin(world, tree, cache, tiles, s.key, f)
                .clone(),
            None => meshes_cache.grid(world, tree, cache, tiles, s.key).clone(),
        };
        tris += m.indices.len() / 3;
        meshes.push(m);
    }
    (
        tris,
        measure::view_error(world, tree, &meshes, cam, per_side),
    )
}

/// Selection where each node's error bound is that of its TIN (grid error + exact TIN delta),
/// so the TIN variant is held to the same threshold honestly.
fn select_tin(
    world: &World,
    tree: &QuadTree,
    ctx: &mut (BoundsCache, TileCache, MeshCache),
    cam: &Camera,
    tau: f64,
    target: f64,
) -> Selection {
    // Both closures need the caches, one after the other; the TIN is built only for nodes that
    // survive culling.
    let ctx = std::cell::RefCell::new(ctx);
    let k = cam.k_px();
    engine::select::traverse(
        tree,
        cam,
        true,
        |key| ctx.borrow_mut().0.get(world, tree, key),
        |key, _, dist, _| {
            let mut c = ctx.borrow_mut();
            let (cache, tiles, meshes) = &mut **c;
            let err = meshes
                .tin(world, tree, cache, tiles, key, target)
                .bounds
                .error_m;
            dist <= 0.0 || err * k / dist > tau
        },
    )
}

struct CurvePoint {
    method: &'static str,
    triangles: f64,
    max_px: f64,
}

fn section_error(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
) -> Vec<CurvePoint> {
    let taus: &[f64] = if quick {
        &[2.0, 8.0]
    } else {
        &[0.5, 1.0, 2.0, 4.0, 8.0]
    };
    let n_cams = if quick { 1 } else { 4 };
    let step = (cams.len() / n_cams).max(1);
    let cams: Vec<Camera> = cams.iter().step_by(step).take(n_cams).copied().collect();
    let per_side = if quick { 12 } else { 24 };
    let tin_target = 0.5;
    let mut ctx = (BoundsCache::new(), TileCache::new(), MeshCache::default());
    let mut curve = Vec::new();
    let b = bar((taus.len() * cams.len()) as u64, "speed vs error");
    for &tau in taus {
        let params = format!(
            "tau {tau} px, {} cameras, lattice {per_side}² per node",
            cams.len()
        );
        let (mut g_tris, mut g_max, mut g_mean) = (0usize, 0.0f64, 0.0f64);
        let (mut t_tris, mut t_max, mut t_mean) = (0usize, 0.0f64, 0.0f64);
        for cam in &cams {
            let sel = select(
                world,
                tree,
                &mut ctx.0,
                cam,
                SelectParams {
                    tau_px: tau,
                    max_level: tree.max_level,
                    cull: true,
                },
            );
            let (tris, e) = measure_view(world, tree, &mut ctx, cam, &sel, per_side, None);
            g_tris += tris;
            g_max = g_max.max(e.max_px);
            g_mean += e.mean_px / cams.len() as f64;
            let sel_t = select_tin(world, tree, &mut ctx, cam, tau, tin_target);
            let (tris, e) = measure_view(
                world,
                tree,
                &mut ctx,
                cam,
                &sel_t,
                per_side,
                Some(tin_target),
            );
            t_tris += tris;
            t_max = t_max.max(e.max_px);
            t_mean += e.mean_px / cams.len() as f64;
            b.inc(1);
        }
        let nc = cams.len() as f64;
        // CDLOD-style baseline: the smallest distance ratio whose measured max error is at most
        // the grid's measured max error (bisection; error falls as the ratio grows).
        let measure_ratio = |ratio: f64, ctx: &mut (BoundsCache, TileCache, MeshCache)| {
            let (mut tris, mut mx, mut mean) = (0usize, 0.0f64, 0.0f64);
            for cam in &cams {
                let sel = measure::select_by_distance(world, tree, &mut ctx.0, cam, ratio);
                let (t, e) = measure_view(world, tree, ctx, cam, &sel, per_side, None);
                tris += t;
                mx = mx.max(e.max_px);
                mean += e.mean_px / nc;
            }
            (tris, mx, mean)
        };
        let (mut lo, mut hi) = (0.25f64, 32.0f64);
        let mut best = measure_ratio(hi, &mut ctx);
        for _ in 0..if quick { 5 } else { 8 } {
            let mid = (lo * hi).sqrt();
            let m = measure_ratio(mid, &mut ctx);
            if m.1 <= g_max {
                hi = mid;
                best = m;
            } else {
                lo = mid;
            }
        }
        r.add(
            "error",
            "grid triangles per frame",
            g_tris as f64 / nc,
            "triangles",
            &params,
        );
        r.add("error", "grid measured max error", g_max, "px", &params);
        r.add("error", "grid measured mean error", g_mean, "px", &params);
        r.add(
            "error",
            "TIN triangles per frame",
            t_tris as f64 / nc,
            "triangles",
            &params,
        );
        r.add("error", "TIN measured max error", t_max, "px", &params);
        r.add("error", "TIN measured mean error", t_mean, "px", &params);
        r.add(
            "error",
            "CDLOD-style triangles per frame",
            best.0 as f64 / nc,
            "triangles",
            &format!("{params}, ratio {hi:.2}"),
        );
        r.add(
            "error",
            "CDLOD-style measured max error",
            best.1,
            "px",
            &format!("{params}, ratio {hi:.2}"),
        );
        r.add(
            "error",
            "CDLOD-style measured mean error",
            best.2,
            "px",
            &format!("{params}, ratio {hi:.2}"),
        );
        curve.push(CurvePoint {
            method: "grid (ours)",
            triangles: g_tris as f64 / nc,
            max_px: g_max,
        });
        curve.push(CurvePoint {
            method: "TIN (ours)",
            triangles: t_tris as f64 / nc,
            max_px: t_max,
        });
        curve.push(CurvePoint {
            method: "CDLOD-style distance",
            triangles: best.0 as f64 / nc,
            max_px: best.1,
        });
    }
    b.finish_and_clear();
    curve
}

/// A closed loop over the map at a fixed height above the ground, sampled at `speed_m_s`
/// for `frames` frames of `dt_s`.
fn loop_path(
    world: &World,
    speed_m_s: f64,
    frames: usize,
    dt_s: f64,
    viewport_px: [u32; 2],
) -> Vec<Camera> {
    let o = world.origin_m();
    let s = world.size_m();
    let (cx, cy) = (o[0] + 0.5 * s[0], o[1] + 0.5 * s[1]);
    let (rx, ry) = (0.32 * s[0], 0.28 * s[1]);
    let circumference = std::f64::consts::TAU * f64::midpoint(rx * rx, ry * ry).sqrt();
    (0..frames)
        .map(|f| {
            let a = std::f64::consts::TAU * (f as f64 * dt_s * speed_m_s / circumference);
            let (x, y) = (cx + rx * a.cos(), cy + ry * a.sin());
            let z = world.height_m(x, y).max(world.map.manifest.water_level_m) + 40.0;
            let tangent = glam::DVec3::new(-rx * a.sin(), ry * a.cos(), 0.0).normalize();
            let dir = (tangent + glam::DVec3::new(0.0, 0.0, -0.25)).normalize();
            let pos = glam::DVec3::new(x, y, z);
            Camera::look_at(pos, pos + dir, 60f64.to_radians(), viewport_px)
        })
        .collect()
}

fn section_streaming(
    world_path: &std::path::Path,
    r: &mut Report,
    quick: bool,
    workers: usize,
    viewport_px: [u32; 2],
) -> Result<()> {
    use engine::stream::{StreamSettings, Streamer, terrain_phases};
    let dt = 1.0 / 60.0;
    let seconds = if quick { 2.0 } else { 12.0 };
    let frames = (seconds / dt) as usize;
    let tau = 2.0;
    for speed in [50.0, 150.0, 300.0] {
        let world = open_world(world_path)?;
        let cams = loop_path(&world, speed, frames, dt, viewport_px);
        let settings = StreamSettings {
            workers: workers.saturating_sub(1).max(1),
            tau_px: tau,
            ..StreamSettings::default()
        };
        let mut s = Streamer::new(world, settings, terrain_phases());
        // Warm start at the first camera, as after loading.
        s.settle(&cams[0], 300.0);
        s.take_latencies();
        let c0 = s.stats.cancelled_queued + s.stats.cancelled_running + s.stats.cancelled_gpu;
        let b = bar(frames as u64, &format!("streaming {speed} m/s"));
        let (mut debt_frames, mut worst_excess, mut frame_times) =
            (0usize, 0.0f64, Vec::with_capacity(frames));
        let start = Instant::now();
        for (f, cam) in cams.iter().enumerate() {
            let t = Instant::now();
            s.update(cam, dt);
            s.run_gpu_phases();
            frame_times.push(t.elapsed().as_secs_f64());
            // Pop debt: a drawn node standing in for nodes that the ideal selection at tau wants
            // (so it is visible and too coarse). Its excess is its error projected at the
            // distance of the visible nodes it stands in for, minus tau.
            let k = cam.k_px();
            let tree = *s.tree();
            let drawn: std::collections::HashSet<NodeKey> =
                s.draw_list().iter().map(|d| d.key).collect();
            let mut excess = 0.0f64;
            for want in s.select_wanted(cam, tau) {
                if drawn.contains(&want) {
                    continue;
                }
                let Some(wb) = s.shared.bounds.peek(want) else {
                    continue;
                };
                let (wmin, wmax) = engine::select::node_aabb(&tree, want, &wb);
                let dist =
                    engine::select::distance_to_aabb(cam.position_m, wmin, wmax).max(cam.near_m);
                let mut a = want.parent();
                while let Some(n) = a {
                    if drawn.contains(&n) {
                        if let Some(nb) = s.shared.bounds.peek(n) {
                            excess = excess.max(nb.error_m * k / dist - tau);
                        }
                        break;
                    }
                    a = n.parent();
                }
            }
            if excess > 0.0 {
                debt_frames += 1;
                worst_excess = worst_excess.max(excess);
            }
            b.inc(1);
            // Real time: frame f ends at (f + 1) * dt.
            let due = (f + 1) as f64 * dt;
            let now = start.elapsed().as_secs_f64();
            if now < due {
                std::thread::sleep(std::time::Duration::from_secs_f64(due - now));
            }
        }
        b.finish_and_clear();
        let mut lat = s.take_latencies();
        lat.sort_by(f64::total_cmp);
        let q = |p: f64| {
            if lat.is_empty() {
                f64::NAN
            } else {
                lat[((lat.len() - 1) as f64 * p).round() as usize]
            }
        };
        let params = format!(
            "{speed} m/s, {seconds} s at 60 Hz, tau {tau} px, {} worker(s)",
            s.settings.workers
        );
        r.add(
            "streaming",
            "request-to-ready latency p50",
            q(0.5) * 1e3,
            "ms",
            &params,
        );
        r.add(
            "streaming",
            "request-to-ready latency p95",
            q(0.95) * 1e3,
            "ms",
            &params,
        );
        r.add(
            "streaming",
            "request-to-ready latency p99",
            q(0.99) * 1e3,
            "ms",
            &params,
        );
        r.add(
            "streaming",
            "jobs completed",
            lat.len() as f64,
            "jobs",
            &params,
        );
        let cancelled =
            s.stats.cancelled_queued + s.stats.cancelled_running + s.stats.cancelled_gpu - c0;
        r.add(
            "streaming",
            "jobs cancelled",
            cancelled as f64,
            "jobs",
            &params,
        );
        r.add(
            "streaming",
            "pop debt (frames with a drawn node over tau)",
            100.0 * debt_frames as f64 / frames as f64,
            "%",
            &params,
        );
        r.add(
            "streaming",
            "worst excess over tau",
            worst_excess,
            "px",
            &params,
        );
        frame_times.sort_by(f64::total_cmp);
        let fq = |p: f64| frame_times[((frame_times.len() - 1) as f64 * p).round() as usize];
        r.add(
            "streaming",
            "bookkeeping per frame p50 (update + GPU phases)",
            fq(0.5) * 1e6,
            "µs",
            &params,
        );
        r.add(
            "streaming",
            "bookkeeping per frame p99",
            fq(0.99) * 1e6,
            "µs",
            &params,
        );
    }
    Ok(())
}

/// Loads a system font for plot labels (plotters' ab_glyph backend needs one in memory).
fn register_font() -> bool {
    for p in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
    ] {
        if let Ok(bytes) = std::fs::read(p) {
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            return plotters::style::register_font(
                "sans-serif",
                plotters::style::FontStyle::Normal,
                bytes,
            )
            .is_ok();
        }
    }
    false
}

fn write_plot(path: &PathBuf, curve: &[CurvePoint]) -> Result<()> {
    use plotters::prelude::*;
    if curve.is_empty() {
        return Ok(());
    }
    if !register_font() {
        bail!("no DejaVuSans.ttf found for plot labels (Debian package fonts-dejavu-core)");
    }
    let (w, h) = (900u32, 600u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let tmax = curve.iter().map(|c| c.triangles).fold(1.0, f64::max) * 1.3;
        let tmin = curve
            .iter()
            .map(|c| c.triangles)
            .fold(f64::INFINITY, f64::min)
            .max(1.0)
            / 1.3;
        let emax = curve.iter().map(|c| c.max_px).fold(0.1, f64::max) * 1.2;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Triangles against measured max pixel error",
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d((tmin..tmax).log_scale(), 0.0..emax)?;
        chart
            .configure_mesh()
            .x_desc("triangles per frame")
            .y_desc("measured max error (px)")
            .draw()?;
        for (i, method) in ["grid (ours)", "TIN (ours)", "CDLOD-style distance"]
            .iter()
            .enumerate()
        {
            let color = Palette99::pick(i).to_rgba();
            let pts: Vec<(f64, f64)> = curve
                .iter()
                .filter(|c| c.method == *method)
                .map(|c| (c.triangles, c.max_px))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(*method)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(f), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()?.write_image_data(&buf)?;
    Ok(())
}

fn machine_block(workers: usize) -> serde_json::Value {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    serde_json::json!({
        "cores": std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get),
        "workers": workers,
        "cpu": cpu,
        "adapter": "none (CPU-only benchmark)",
    })
}

fn open_world(path: &std::path::Path) -> Result<World> {
    // The viewer's: generates the default map when missing or from an older map format.
    engine::app::open_world(path, &worldgen::progress::Silent)
        .with_context(|| format!("opening map {}", path.display()))
}

fn run(cli: &Cli) -> Result<()> {
    for s in &cli.only {
        if !SECTIONS.contains(&s.as_str()) {
            bail!("unknown section {s:?}; choose from {}", SECTIONS.join(", "));
        }
    }
    let want = |s: &str| cli.only.is_empty() || cli.only.iter().any(|o| o == s);
    let workers = cli
        .workers
        .unwrap_or_else(|| {
            std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
        })
        .max(1);
    let world = open_world(&cli.map)?;
    let tree = QuadTree::new(world.origin_m(), world.size_m());
    let vh = cli.viewport_height.max(16);
    let cams = measure::default_flight(&world, if cli.quick { 8 } else { 64 }, [vh * 16 / 9, vh]);
    let mut report = Report { rows: Vec::new() };
    let t0 = Instant::now();
    if want("tiles") {
        section_tiles(&world, &mut report, cli.quick, workers);
    }
    if want("terrain") {
        section_terrain(&world, &tree, &cams, &mut report, cli.quick, workers);
    }
    if want("selection") {
        section_selection(&world, &tree, &cams, &mut report, cli.quick);
    }
    let mut curve = Vec::new();
    if want("error") {
        curve = section_error(&world, &tree, &cams, &mut report, cli.quick);
    }
    if want("vegetation") {
        section_vegetation(&world, &tree, &cams, &mut report, cli.quick);
    }
    if want("streaming") {
        section_streaming(&cli.map, &mut report, cli.quick, workers, [vh * 16 / 9, vh])?;
    }
    println!(
        "nodebench on {} ({} x {} m, {} levels), {} worker(s), {:.1} s{}\n",
        cli.map.display(),
        world.size_m()[0],
        world.size_m()[1],
        tree.max_level + 1,
        workers,
        t0.elapsed().as_secs_f64(),
        if cli.quick { ", --quick" } else { "" }
    );
    report.print_markdown();
    if !curve.is_empty() {
        match write_plot(&cli.plot, &curve) {
            Ok(()) => println!("\nplot: {}", cli.plot.display()),
            Err(e) => eprintln!("warning: plot not written: {e:#}"),
        }
    }
    if let Some(p) = &cli.json {
        let doc = serde_json::json!({ "machine": machine_block(workers), "rows": report.rows });
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::write(p, serde_json::to_string_pretty(&doc)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("json: {}", p.display());
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    match run(&Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
