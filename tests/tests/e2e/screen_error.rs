//! The pixel bound on the screen: a cliff in each corner of wide screens, measured through the
//! camera's matrices (engine::measure), against the selection's bound (engine::terrain::select).

use engine::camera::Camera;
use engine::measure::{self, ScreenRegion};
use engine::surface::world::World;
use engine::terrain::bounds::BoundsCache;
use engine::terrain::quadtree::QuadTree;
use engine::terrain::select::{SelectParams, select};
use engine::terrain::tiles::TileCache;
use glam::DVec3;
use tests::terrain::{build_selection, cliff_world, tree_of};

/// The x of the cliff face in the cliff world (100 m up between the samples at 156 and 160 m).
const CLIFF_X_M: f64 = 158.0;

/// A camera whose view puts the cliff's top edge at `at_y_m` near the screen corner
/// (`sx`, `sy` = ±1: right/left, top/bottom), 90 % of the way from the centre to the corner, seen
/// from `dist_m` away on the low side of the cliff.
fn corner_camera(
    world: &World,
    fovy_deg: f64,
    viewport: [u32; 2],
    (sx, sy): (f64, f64),
    at_y_m: f64,
    dist_m: f64,
) -> Camera {
    let top = DVec3::new(CLIFF_X_M, at_y_m, world.height_m(CLIFF_X_M + 2.0, at_y_m));
    // Looking across the cliff (east, turned away from the corner's side so the cliff stays in
    // view) and down for a top corner, level for a bottom one.
    let yaw = sx * 0.35;
    let pitch: f64 = if sy > 0.0 { -0.55 } else { -0.05 };
    let fwd = DVec3::new(
        yaw.cos() * pitch.cos(),
        yaw.sin() * pitch.cos(),
        pitch.sin(),
    );
    let probe = Camera::look_at(DVec3::ZERO, fwd, fovy_deg.to_radians(), viewport);
    let ty = (probe.fovy_rad * 0.5).tan();
    let tx = ty * probe.aspect();
    let ray =
        (probe.forward - 0.9 * sx * tx * probe.right() + 0.9 * sy * ty * probe.up).normalize();
    let eye = top - ray * dist_m;
    Camera::look_at(eye, eye + fwd, probe.fovy_rad, viewport)
}

/// The on-screen error of a selection: the largest over dense samples of its meshes, and by
/// screen region.
fn on_screen_error(
    world: &World,
    tree: &QuadTree,
    cache: &mut BoundsCache,
    tiles: &mut TileCache,
    cam: &Camera,
    params: SelectParams,
) -> (measure::ViewError, u32) {
    let sel = select(world, tree, cache, cam, params);
    let meshes = build_selection(world, tree, cache, tiles, &sel);
    let samples: Vec<_> = sel
        .nodes
        .iter()
        .filter(|s| s.error_px <= params.tau_px)
        .map(|s| measure::node_error_samples(world, tree, &meshes[&s.key], 4))
        .collect();
    let refs: Vec<_> = samples.iter().collect();
    (
        measure::view_max_error_px(&refs, cam, true),
        sel.over_tau_at_finest,
    )
}

/// At 90 and 120 degrees, with the cliff in each corner of the screen: the error measured on
/// the screen stays within tau; the same views selected with the on-axis bound (the former
/// metric, which leaves out the off-axis stretch) show more than tau there, so this test fails
/// without the stretch.
#[test]
fn a_cliff_in_each_screen_corner_stays_within_tau_on_the_screen() {
    let world = cliff_world();
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    let viewport = [320, 180];
    let tau = 2.0;
    let (mut worst, mut worst_on_axis_corner) = (0.0f64, 0.0f64);
    for fovy_deg in [90.0, 120.0] {
        for corner in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
            let cam = corner_camera(&world, fovy_deg, viewport, corner, 300.0, 60.0);
            let ground = world.height_m(cam.position_m.x, cam.position_m.y);
            assert!(
                cam.position_m.z > ground + 2.0,
                "{fovy_deg} {corner:?}: the camera is under the ground"
            );
            let p = SelectParams::culled(tau, &tree);
            let (e, over) = on_screen_error(&world, &tree, &mut cache, &mut tiles, &cam, p);
            assert!(
                e.samples > 10_000,
                "{fovy_deg} {corner:?}: {} samples",
                e.samples
            );
            assert!(
                e.max_px <= tau,
                "{fovy_deg} deg, corner {corner:?}: {:.3} px on the screen over tau {tau} \
                 (by region {:?}; {over} finest nodes over tau left out)",
                e.max_px,
                e.region_max_px
            );
            worst = worst.max(e.max_px);
            let axis = SelectParams {
                off_axis: false,
                ..p
            };
            let (a, _) = on_screen_error(&world, &tree, &mut cache, &mut tiles, &cam, axis);
            worst_on_axis_corner =
                worst_on_axis_corner.max(a.region_max_px[ScreenRegion::Corners as usize]);
        }
    }
    // The views are hard: the bound is not met by accident far under tau.
    assert!(
        worst > 0.4 * tau,
        "largest on-screen error only {worst:.3} px"
    );
    assert!(
        worst_on_axis_corner > tau,
        "the on-axis bound held in the corners too ({worst_on_axis_corner:.3} px)"
    );
}
