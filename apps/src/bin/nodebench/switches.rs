//! Vegetation rows: the image error of the representation switches (mesh, billboard, group
//! billboard, left out), drawn at the nearest distance the selection shows each node from and
//! measured as the distance between the two silhouettes, per transition, against tau.

use crate::report::{Report, bar};
use engine::camera::Camera;
use engine::surface::World;
use engine::switch_error::{SwitchError, SwitchRig};
use engine::terrain::quadtree::{NodeKey, QuadTree};
use engine::vegetation::Placer;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Each view is drawn this many times as finely per side (the silhouettes' quantization is a
/// third of a pixel).
const SUPERSAMPLE: u32 = 3;

/// Compass directions the camera looks at each node from (0: south, the billboards' view).
const AZIMUTHS_DEG: [f64; 4] = [0.0, 45.0, 90.0, 180.0];

/// The nodes measured: those holding `cams`' ground positions at every level that has
/// vegetation of its own, coarsest first, without repeats.
fn nodes(world: &World, tree: &QuadTree, placer: &Placer, cams: &[Camera]) -> Vec<NodeKey> {
    let mut keys = Vec::new();
    for c in cams {
        for level in 0..tree.max_level {
            if let Some(k) = tree.key_at(level, c.position_m.x, c.position_m.y)
                && !keys.contains(&k)
                && engine::vegetation::node_vegetation(world, placer, tree, k).instances() > 0
            {
                keys.push(k);
            }
        }
    }
    keys
}

pub(crate) fn switch_rows(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
) {
    let Some((g, adapter)) = crate::gpu::adapter() else {
        eprintln!("no GPU adapter: the vegetation switch rows left out");
        return;
    };
    let placer = Placer::new(world);
    let cams = &cams[..cams.len().min(if quick { 1 } else { 2 })];
    let keys = nodes(world, tree, &placer, cams);
    let fovy_rad = cams[0].fovy_rad;
    let mut rig = SwitchRig::new(&g, &placer, cams[0].viewport_px, fovy_rad, SUPERSAMPLE);
    let taus: &[f64] = if quick { &[2.0] } else { &[2.0, 1.0] };
    for &tau_px in taus {
        let b = bar(
            keys.len() as u64,
            &format!("vegetation switches, tau {tau_px}"),
        );
        let mut all: Vec<SwitchError> = Vec::new();
        for &k in &keys {
            match rig.measure_node(&g, world, &placer, tree, k, tau_px, &AZIMUTHS_DEG) {
                Ok(v) => all.extend(v),
                Err(e) => b.println(format!("vegetation switch of {k:?}: {e}")),
            }
            b.inc(1);
        }
        b.finish_and_clear();
        let mut by: BTreeMap<String, Vec<&SwitchError>> = BTreeMap::new();
        for e in &all {
            by.entry(e.transition.label()).or_default().push(e);
        }
        for (label, v) in by {
            let worst = v
                .iter()
                .max_by(|a, b| a.silhouette.max_px.total_cmp(&b.silhouette.max_px))
                .expect("a transition has a measurement");
            let p99 = v.iter().map(|e| e.silhouette.p99_px).fold(0.0, f64::max);
            let spacings: Vec<f64> = {
                let mut s: Vec<f64> = v.iter().map(|e| e.spacing_m).collect();
                s.sort_by(f64::total_cmp);
                s.dedup();
                s
            };
            let mut params = format!(
                "tau {tau_px} px, {} nodes of spacing {}..{} m x {} directions, {}x{} px \
                 drawn {SUPERSAMPLE}x{SUPERSAMPLE} as finely, {:.0} deg, on {adapter}; worst: \
                 spacing {} m, from {} deg at {:.1} m, {} / {} items",
                v.len() / AZIMUTHS_DEG.len(),
                spacings[0],
                spacings[spacings.len() - 1],
                AZIMUTHS_DEG.len(),
                cams[0].viewport_px[0],
                cams[0].viewport_px[1],
                fovy_rad.to_degrees(),
                worst.spacing_m,
                worst.azimuth_deg,
                worst.distance_m,
                worst.items[0],
                worst.items[1],
            );
            let _ = write!(params, "; max by spacing:");
            for s in &spacings {
                let at = v
                    .iter()
                    .filter(|e| e.spacing_m == *s)
                    .map(|e| e.silhouette.max_px)
                    .fold(0.0, f64::max);
                let _ = write!(params, " {s} m {at:.1} px,");
            }
            params.pop();
            if worst.silhouette.max_px > tau_px {
                let _ = write!(params, "; above tau");
            }
            r.add(
                "vegetation",
                &format!("switch image error, {label}: max"),
                worst.silhouette.max_px,
                "px",
                &params,
            );
            r.add(
                "vegetation",
                &format!("switch image error, {label}: largest p99 of a view"),
                p99,
                "px",
                &params,
            );
        }
    }
}
