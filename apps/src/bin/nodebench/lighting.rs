//! Section `lighting`: light grids against the ray-marched reference (the share of points whose
//! sky, sun visibility and ground bounce agree within the tolerance), computation time per grid
//! (in full, and from the grid's sky page), bytes per grid, and the time the lighting kind's
//! threads take to light every grid the flight's drawn nodes hold: the first time (baking their
//! sky pages), again from the pages, and after a sun change.

use crate::report::{Report, bar};
use crate::terrain::flight_nodes;
use engine::camera::Camera;
use engine::lighting::content::LightingContent;
use engine::lighting::grid::{COLUMNS, GROUND_LAYER_M, LightGrid, Sun, grid_level};
use engine::lighting::reference;
use engine::lighting::sky_pages::{PAYLOAD_BYTES, SkyPages};
use engine::stream::ContentKind;
use engine::surface::World;
use engine::terrain::quadtree::{NodeKey, QuadTree};
use engine::vegetation::Placer;
use engine::vegetation::canopy::Canopy;
use std::sync::Arc;
use std::time::Instant;
use worldgen::noise::unit3;

/// Where the section keeps the sky pages it writes (emptied at its start).
const PAGES_DIR: &str = "target/nodebench/sky_pages";

/// Bytes of the files under `dir`.
fn walk_bytes(dir: &std::path::Path) -> u64 {
    std::fs::read_dir(dir).map_or(0, |entries| {
        entries
            .flatten()
            .map(|e| match e.metadata() {
                Ok(m) if m.is_dir() => walk_bytes(&e.path()),
                Ok(m) => m.len(),
                Err(_) => 0,
            })
            .sum()
    })
}

/// Agreement tolerance on a visibility (see tests/tests/e2e/lighting.rs for why).
const TOLERANCE: f64 = 0.05;

/// A low morning sun in the east.
const SUN: Sun = Sun {
    azimuth_deg: 100.0,
    elevation_deg: 15.0,
};

pub(crate) fn section_lighting(
    world: &Arc<World>,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
    workers: usize,
) {
    let canopy = Canopy::new(world, &Placer::new(world));
    let level = grid_level(tree);
    // The grid nodes the flight needs: the ancestors at the grid level of its selected nodes.
    let mut keys: Vec<NodeKey> = flight_nodes(world, tree, cams, usize::MAX)
        .into_iter()
        .filter(|k| k.level >= level)
        .map(|k| k.ancestor_at(level))
        .collect();
    keys.sort();
    keys.dedup();
    if quick {
        keys.truncate(8);
    }
    if keys.is_empty() {
        eprintln!("lighting: the flight needs no light grid on this map; section left out");
        return;
    }
    let params = format!(
        "{} grids of the flight's selections (tau 2), sun azimuth {} deg, elevation {} deg",
        keys.len(),
        SUN.azimuth_deg,
        SUN.elevation_deg
    );

    // Computation per grid, one core.
    let timed = keys.len().min(if quick { 3 } else { 24 });
    let step = (keys.len() / timed.max(1)).max(1);
    let sample: Vec<NodeKey> = keys.iter().copied().step_by(step).take(timed).collect();
    let b = bar(sample.len() as u64, "light grids");
    let mut secs = Vec::new();
    let mut grids = Vec::new();
    for &key in &sample {
        let t0 = Instant::now();
        let g = LightGrid::compute(world, &canopy, tree, key, SUN);
        secs.push(t0.elapsed().as_secs_f64());
        grids.push(g);
        b.inc(1);
    }
    b.finish_and_clear();
    r.timings(
        "lighting",
        "grid computation",
        secs,
        &format!("{} of the {params} (grid level), 1 core", sample.len()),
    );
    // Coarser grids (each column computed as at the grid level, so the lattice near their
    // columns costs more): the ancestors of the first timed grid, one level up and two.
    for up in 1..=2u8 {
        let Some(key) = sample
            .first()
            .filter(|k| k.level >= up)
            .map(|k| k.ancestor_at(k.level - up))
        else {
            continue;
        };
        let t0 = Instant::now();
        let _ = LightGrid::compute(world, &canopy, tree, key, SUN);
        r.add(
            "lighting",
            &format!("grid computation, {up} level(s) coarser"),
            t0.elapsed().as_secs_f64() * 1e3,
            "ms",
            &format!("one {} m grid, 1 core", tree.node_size_m(key.level)),
        );
    }
    grids_from_pages(world, &canopy, tree, &grids, r);
    if let Some(g) = grids.first() {
        r.add(
            "lighting",
            "bytes per grid",
            g.bytes() as f64,
            "B",
            "heights f32 + sky, canopy transmittance toward the sun, sun margin and bounce u8 per sample",
        );
    }

    reference_agreement(world, &canopy, tree, &grids, r, quick);

    light_the_flight(world, canopy, tree, cams, r, (quick, workers));
}

/// The sample `grids` made again from their sky pages (written here from the grids, read back
/// from the disk), as a node is made once its page is baked: time per grid, and whether each
/// equals the full computation.
fn grids_from_pages(
    world: &Arc<World>,
    canopy: &Canopy,
    tree: &QuadTree,
    grids: &[LightGrid],
    r: &mut Report,
) {
    let pages_dir = std::path::Path::new(PAGES_DIR);
    let _ = std::fs::remove_dir_all(pages_dir);
    let pages = SkyPages::new(pages_dir, world, canopy);
    let b = bar(grids.len() as u64, "light grids from sky pages");
    let mut page_secs = Vec::new();
    let mut equal = 0;
    for g in grids {
        if let Err(e) = pages.write(g) {
            eprintln!(
                "lighting: cannot write {} ({e})",
                pages.path(g.key).display()
            );
        }
        let t0 = Instant::now();
        let from_page = pages.grid((world, canopy, tree), g.key, SUN);
        page_secs.push(t0.elapsed().as_secs_f64());
        equal += usize::from(from_page == *g);
        b.inc(1);
    }
    b.finish_and_clear();
    r.timings(
        "lighting",
        "grid from its sky page",
        page_secs,
        &format!(
            "the same {} grids, each page read from the disk and the rest computed, 1 core; {equal} \
             of {} equal to the full computation",
            grids.len(),
            grids.len()
        ),
    );
}

/// Lights, by the lighting kind's own threads, every grid the flight's drawn nodes and their
/// ancestors hold (the coarser nodes own theirs): the first computation (which bakes their sky
/// pages), a second visit from the pages, and a relight after a sun change.
fn light_the_flight(
    world: &Arc<World>,
    canopy: Canopy,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    (quick, workers): (bool, usize),
) {
    let level = grid_level(tree);
    let pages_dir = std::path::Path::new(PAGES_DIR);
    let mut all: Vec<NodeKey> = flight_nodes(world, tree, cams, usize::MAX)
        .into_iter()
        .flat_map(|k| std::iter::once(k).chain(k.ancestors()))
        .map(|k| LightGrid::owner(tree, k))
        .collect();
    all.sort();
    all.dedup();
    if quick {
        all.truncate(8);
    }
    let canopy = Arc::new(canopy);
    let _ = std::fs::remove_dir_all(pages_dir);
    let kind = LightingContent::with_threads(world, Arc::clone(&canopy), SUN, workers);
    kind.keep_sky_pages_in(pages_dir);
    // No streamer here: the kind shares the benchmark's world.
    kind.attach_world(world);
    let t0 = Instant::now();
    let held: Vec<_> = all.iter().map(|&k| kind.grid_for(k)).collect();
    kind.wait_idle();
    let first_s = t0.elapsed().as_secs_f64();
    // A second visit: a new kind (no grid held) whose pages the first one baked.
    let again = LightingContent::with_threads(world, canopy, SUN, workers);
    again.keep_sky_pages_in(pages_dir);
    again.attach_world(world);
    let t0 = Instant::now();
    let held_again: Vec<_> = all.iter().map(|&k| again.grid_for(k)).collect();
    again.wait_idle();
    let again_s = t0.elapsed().as_secs_f64();
    drop(held_again);
    let page_bytes: u64 = walk_bytes(pages_dir);
    let sun = Sun {
        azimuth_deg: SUN.azimuth_deg + 30.0,
        ..SUN
    };
    let t0 = Instant::now();
    kind.set_sun(sun);
    kind.wait_idle();
    let relight_s = t0.elapsed().as_secs_f64();
    assert!(
        held.iter()
            .all(|g| g.grid().is_some_and(|g| g.sun_dir == sun))
    );
    let params = format!(
        "the {} grids the flight's drawn nodes and their ancestors hold ({} at the grid level, \
         {} coarser), {} light thread(s)",
        all.len(),
        all.iter().filter(|k| k.level == level).count(),
        all.iter().filter(|k| k.level < level).count(),
        kind.threads()
    );
    r.add(
        "lighting",
        "light every grid of the flight (first computation)",
        first_s * 1e3,
        "ms",
        &format!("{params}; each writes its sky page"),
    );
    r.add(
        "lighting",
        "light every grid of the flight from their sky pages",
        again_s * 1e3,
        "ms",
        &format!("{params}; a second visit: the pages the first computation wrote"),
    );
    r.add(
        "lighting",
        "sky pages of the flight on disk",
        page_bytes as f64 / (1024.0 * 1024.0),
        "MiB",
        &format!("{} pages of {} B", all.len(), PAYLOAD_BYTES),
    );
    r.add(
        "lighting",
        "relight every grid of the flight after a sun change",
        relight_s * 1e3,
        "ms",
        &format!("{params}; azimuth turned by 30 deg"),
    );
}

/// Agreement with the reference on random points of `grids`: the share of points whose sky and
/// whose sun visibility are within [`TOLERANCE`], interpolated as the shaders do and at the
/// nearest grid sample.
fn reference_agreement(
    world: &World,
    canopy: &Canopy,
    tree: &QuadTree,
    grids: &[LightGrid],
    r: &mut Report,
    quick: bool,
) {
    // Agreement with the reference on random points of the timed grids.
    let points = if quick { 40 } else { 300 };
    let b = bar(points as u64, "lighting reference");
    let (mut sky_ok, mut sun_ok) = (0usize, 0usize);
    // The same at the grid sample nearest to each point (no interpolation): what the
    // computation itself gets right, apart from the grid's resolution.
    let (mut sky_at_sample, mut sun_at_sample) = (0usize, 0usize);
    // The ground's bounce on every third point: within the tolerance, and within 0.02.
    let (mut bounce_n, mut bounce_ok, mut bounce_close) = (0usize, 0usize, 0usize);
    for i in 0..points {
        let g = &grids[i % grids.len()];
        let rect = tree.rect(g.key);
        let x = rect.min[0] + (rect.max[0] - rect.min[0]) * unit3(17, i as i64, 0);
        let y = rect.min[1] + (rect.max[1] - rect.min[1]) * unit3(17, i as i64, 1);
        // From the ground to a third above the canopy's top.
        let hi = 1.3 * g.layers_m[g.layers_m.len() - 1];
        let above = GROUND_LAYER_M + (hi - GROUND_LAYER_M) * unit3(17, i as i64, 2).powi(2);
        let (g_sky, g_sun) = g.sample(x, y, above);
        let (r_sky, r_sun) = reference::visibility(world, canopy, x, y, above, SUN);
        sky_ok += usize::from((g_sky - r_sky).abs() <= TOLERANCE);
        sun_ok += usize::from((g_sun - r_sun).abs() <= TOLERANCE);
        if i % 3 == 0 {
            let d =
                (g.sample_bounce(x, y, above) - reference::bounce(world, x, y, above, SUN)).abs();
            bounce_n += 1;
            bounce_ok += usize::from(d <= TOLERANCE);
            bounce_close += usize::from(d <= 0.02);
        }
        let last = (COLUMNS - 1) as f64;
        let col = ((x - g.origin_m[0]) / g.spacing_m).round().clamp(0.0, last) as usize;
        let row = ((y - g.origin_m[1]) / g.spacing_m).round().clamp(0.0, last) as usize;
        let layer = (0..g.layers_m.len())
            .min_by(|&a, &b| {
                (g.layers_m[a] - above)
                    .abs()
                    .total_cmp(&(g.layers_m[b] - above).abs())
            })
            .unwrap_or(0);
        let k = LightGrid::index(layer, row, col);
        let (s_sky, s_sun) = reference::visibility(
            world,
            canopy,
            g.origin_m[0] + col as f64 * g.spacing_m,
            g.origin_m[1] + row as f64 * g.spacing_m,
            g.layers_m[layer],
            SUN,
        );
        let (g_sky, g_sun) = g.at_sample(k);
        sky_at_sample += usize::from((g_sky - s_sky).abs() <= TOLERANCE);
        sun_at_sample += usize::from((g_sun - s_sun).abs() <= TOLERANCE);
        b.inc(1);
    }
    b.finish_and_clear();
    let share = |ok: usize| 100.0 * ok as f64 / points as f64;
    let ref_params = format!(
        "{points} random points in {} grids, heights from the ground to 1.3 x the canopy top, tolerance {TOLERANCE}, \
         reference: {} azimuths x {} bands marched on the finest surface",
        grids.len(),
        reference::REF_AZIMUTHS,
        reference::REF_BANDS
    );
    r.add(
        "lighting",
        "sky visibility within tolerance of the reference",
        share(sky_ok),
        "%",
        &ref_params,
    );
    r.add(
        "lighting",
        "sun visibility within tolerance of the reference",
        share(sun_ok),
        "%",
        &ref_params,
    );
    let bounce_params = format!(
        "{bounce_n} of the points (every third), reference: the first terrain hit of {} x {} \
         rays marched on the finest surface, its normal facing the sun",
        reference::REF_AZIMUTHS,
        reference::REF_BANDS
    );
    let bounce_share = |ok: usize| 100.0 * ok as f64 / bounce_n.max(1) as f64;
    r.add(
        "lighting",
        "ground bounce within tolerance of the reference",
        bounce_share(bounce_ok),
        "%",
        &format!("{bounce_params}, tolerance {TOLERANCE}"),
    );
    r.add(
        "lighting",
        "ground bounce within 0.02 of the reference",
        bounce_share(bounce_close),
        "%",
        &bounce_params,
    );
    let sample_params = format!(
        "{ref_params}; at the grid sample nearest to each point, its stored value against the \
         reference there (no interpolation)"
    );
    r.add(
        "lighting",
        "sky visibility within tolerance at the grid's own samples",
        share(sky_at_sample),
        "%",
        &sample_params,
    );
    r.add(
        "lighting",
        "sun visibility within tolerance at the grid's own samples",
        share(sun_at_sample),
        "%",
        &sample_params,
    );
}
