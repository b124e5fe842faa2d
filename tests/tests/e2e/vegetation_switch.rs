//! The image error of vegetation's representation switches, measured on frames drawn on the
//! GPU (`engine::switch_error`): the measure sees what a switch changes, and what it sees
//! shrinks as the camera moves away.

use engine::switch_error::{SwitchError, SwitchRig};
use engine::terrain::quadtree::QuadTree;
use engine::vegetation::{Placer, node_vegetation};

/// Every node holding the map's centre that has vegetation, measured at `tau_px` from the
/// south and the east in a 640 x 360 view drawn 4 x 4 times as finely.
fn measured(tau_px: f64) -> Option<Vec<SwitchError>> {
    let g = tests::gpu::device()?;
    let world = tests::terrain::patches_world();
    let tree = QuadTree::new(world.origin_m(), world.size_m());
    let placer = Placer::new(&world);
    let (o, s) = (world.origin_m(), world.size_m());
    let (x, y) = (o[0] + 0.5 * s[0], o[1] + 0.5 * s[1]);
    let mut rig = SwitchRig::new(&g, &placer, [640, 360], 60f64.to_radians(), 4);
    let mut out = Vec::new();
    for level in 0..tree.max_level {
        let k = tree.key_at(level, x, y).expect("the centre is on the map");
        if node_vegetation(&world, &placer, &tree, k).instances() == 0 {
            continue;
        }
        out.extend(
            rig.measure_node(&g, &world, &placer, &tree, k, tau_px, &[0.0, 90.0])
                .expect("measured"),
        );
    }
    Some(out)
}

/// The largest measured distance of each transition.
fn worst_by_transition(v: &[SwitchError]) -> std::collections::BTreeMap<String, f64> {
    let mut m = std::collections::BTreeMap::new();
    for e in v {
        let w = m.entry(e.transition.label()).or_insert(0.0f64);
        *w = w.max(e.silhouette.max_px);
    }
    m
}

#[test]
fn switches_are_measured_and_shrink_with_distance() {
    let (Some(near), Some(far)) = (measured(2.0), measured(0.5)) else {
        return;
    };
    for e in &near {
        println!(
            "{:<32} spacing {:>6} m from {:>3} deg at {:>8.1} m: {:>5} / {:<5} items, \
             max {:.2} px, p99 {:.2} px",
            e.transition.label(),
            e.spacing_m,
            e.azimuth_deg,
            e.distance_m,
            e.items[0],
            e.items[1],
            e.silhouette.max_px,
            e.silhouette.p99_px
        );
        // Where both sides draw them, the node and its children hold the same items.
        if e.transition.coarse.is_some() && e.transition.fine.is_some() {
            assert_eq!(e.items[0], e.items[1], "{e:?}");
        }
        // Left-out items collapse to their ground points: a finite distance.
        assert!(e.silhouette.max_px.is_finite(), "{e:?}");
        assert!(
            e.silhouette.covered_px[0] + e.silhouette.covered_px[1] > 0,
            "{e:?}"
        );
    }
    let (near_worst, far_worst) = (worst_by_transition(&near), worst_by_transition(&far));
    println!("worst at tau 2 (the switch distance): {near_worst:?}");
    println!("worst at tau 0.5 (four times as far): {far_worst:?}");
    // The ladder's every step happens somewhere on this map, and each shows on the screen.
    for t in [
        "billboard -> mesh",
        "group billboard -> billboard",
        "left out -> group billboard",
    ] {
        let w = near_worst.get(t).copied().unwrap_or(0.0);
        assert!(w >= 1.0, "{t}: {w} px");
    }
    // Four times as far, the same switches move the silhouettes by about a quarter as much
    // (a pixel more for the raster and the items' ground points).
    for (t, w) in &near_worst {
        let f = far_worst.get(t).copied().unwrap_or(0.0);
        assert!(
            f <= 0.25 * w + 1.0,
            "{t}: {w} px near, {f} px four times as far"
        );
    }
}
