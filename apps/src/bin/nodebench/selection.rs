//! Section `selection`: per-frame quad-tree selection along the flight at several thresholds.

use crate::report::{Report, bar};
use engine::camera::Camera;
use engine::surface::World;
use engine::terrain::bounds::BoundsCache;
use engine::terrain::mesh::grid_indices;
use engine::terrain::quadtree::QuadTree;
use engine::terrain::select::{SelectParams, Selection, select};
use std::time::Instant;

/// Triangles drawn for a selection of grid nodes, each with its decimation (32 x 32 x 2 surface
/// + 4 x 32 x 2 skirt triangles undecimated, a quarter as many surface ones per halving).
pub(crate) fn triangles(sel: &Selection) -> usize {
    sel.nodes
        .iter()
        .map(|s| grid_indices(s.decimation).indices.len() / 3)
        .sum()
}

/// The same selection's triangles with every node drawn through all its vertices.
fn triangles_undecimated(sel: &Selection) -> usize {
    sel.nodes.len() * grid_indices(0).indices.len() / 3
}

pub(crate) fn section_selection(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    view: &str,
    r: &mut Report,
    quick: bool,
) {
    let mut cache = BoundsCache::new();
    let taus: &[f64] = if quick { &[2.0] } else { &[1.0, 2.0, 4.0] };
    for &tau in taus {
        let p = SelectParams::culled(tau, tree);
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
            "tau {tau} px, {view}, {} cameras, {}x{}",
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
        let (mut nodes, mut tris, mut full, mut over) = (0usize, 0usize, 0usize, 0u32);
        let mut visited = 0u64;
        let reps = if quick { 3 } else { 10 };
        for _ in 0..reps {
            for cam in cams {
                let t = Instant::now();
                let s = select(world, tree, &mut cache, cam, p);
                times.push(t.elapsed().as_secs_f64());
                nodes += s.nodes.len();
                visited += u64::from(s.visited);
                tris += triangles(&s);
                full += triangles_undecimated(&s);
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
            "nodes visited per frame",
            visited as f64 / frames,
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
            "triangles per frame without decimation",
            full as f64 / frames,
            "triangles",
            &format!("{params}, every node through all its 33 x 33 vertices"),
        );
        // What the off-axis stretch costs: the same cameras with the former on-axis bound.
        let former = SelectParams {
            off_axis: false,
            ..p
        };
        let (mut on_axis_tris, mut on_axis_times, mut on_axis_visited) = (0usize, Vec::new(), 0u64);
        for _ in 0..reps {
            for cam in cams {
                let t = Instant::now();
                let s = select(world, tree, &mut cache, cam, former);
                on_axis_times.push(t.elapsed().as_secs_f64());
                on_axis_tris += triangles(&s);
                on_axis_visited += u64::from(s.visited);
            }
        }
        r.timings(
            "selection",
            "selection per frame with the on-axis bound (bounds cached)",
            on_axis_times,
            &params,
        );
        r.add(
            "selection",
            "nodes visited per frame with the on-axis bound",
            on_axis_visited as f64 / frames,
            "nodes",
            &params,
        );
        r.add(
            "selection",
            "triangles per frame with the on-axis bound (not held on the screen)",
            on_axis_tris as f64 / frames,
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
